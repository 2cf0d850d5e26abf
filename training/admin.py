from django.contrib import admin

from training.models import Quota, QuotaDefaults, RewardFunction, RLModel, Track, Vehicle


@admin.register(Track)
class TrackAdmin(admin.ModelAdmin):
    list_display = ["display_name", "name", "difficulty", "length_m", "width_m"]
    list_filter = ["difficulty"]
    search_fields = ["name", "display_name"]


@admin.register(RLModel)
class RLModelAdmin(admin.ModelAdmin):
    list_display = ["name", "owner", "track", "status", "created_at"]
    list_filter = ["status", "track"]
    search_fields = ["name", "owner__username"]
    date_hierarchy = "created_at"
    list_select_related = ["owner", "track"]


@admin.register(RewardFunction)
class RewardFunctionAdmin(admin.ModelAdmin):
    list_display = ["name", "owner", "updated_at"]
    search_fields = ["name", "owner__username"]
    list_select_related = ["owner"]
    readonly_fields = ["created_at", "updated_at"]


@admin.register(Vehicle)
class VehicleAdmin(admin.ModelAdmin):
    list_display = ["name", "owner", "camera", "lidar", "shell_colour"]
    list_filter = ["camera", "lidar"]
    search_fields = ["name", "owner__username"]


@admin.register(QuotaDefaults)
class QuotaDefaultsAdmin(admin.ModelAdmin):
    """One row: what new racers get."""

    list_display = ["__str__", "max_models", "max_minutes_per_month"]

    def has_add_permission(self, request) -> bool:
        return not QuotaDefaults.objects.exists()

    def has_delete_permission(self, request, obj=None) -> bool:
        return False


@admin.register(Quota)
class QuotaAdmin(admin.ModelAdmin):
    list_display = ["racer", "max_models", "max_minutes_per_month"]
    search_fields = ["racer__username"]
    list_select_related = ["racer"]
    autocomplete_fields = ["racer"]
